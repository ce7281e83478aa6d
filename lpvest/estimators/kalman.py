"""The exact LPV Kalman filter in innovation form, Cox & Tóth (4a)-(4e).

For the affine LPV model with general noise (000_dc6273d4fec795cd.txt, (1)-(3))::

    x_{t+1} = A(p_t) x_t + B(p_t) u_t + G(p_t) w_t
    y_t     = C(p_t) x_t + D(p_t) u_t + H(p_t) v_t,     [w; v] ~ N(0, [[Q, S], [S^T, R]])

with ``x_0 ~ N(x0, P0)``, the one-step predictor in innovation form is

- (4b) ``xi_t = y_t - C x^_{t|t-1} - D u_t`` (innovation),
- (4e) ``Omega_t = C P_{t|t-1} C^T + H R H^T``,
- (4c) ``K_t = (A P_{t|t-1} C^T + G S H^T) Omega_t^-1``,
- (4a) ``x^_{t+1|t} = A x^_{t|t-1} + B u_t + K_t xi_t``,
- (4d) ``P_{t+1|t} = A P A^T - K_t Omega_t K_t^T + G Q G^T``,

all matrices at ``p_t``. The filtered estimate uses the *filter* gain
``L_t = P_{t|t-1} C^T Omega_t^-1`` (ERRATA (7)): ``x^_{t|t} = x^_{t|t-1} + L_t xi_t``.

Numerics
--------
With ``e = x_t - x^_{t|t-1}`` (covariance ``P``), the stacked vector
``z = [A e + G w_t; e; C e + H v_t]`` has covariance
``V = E P E^T + W``, ``E = [A; I; C]``,
``W = [[G Q G^T, 0, G S H^T], [0, 0, 0], [H S^T G^T, 0, H R H^T]]``.
Its blocks hold ``Omega_t`` and ``[A P C^T + G S H^T; P C^T]``, so
``[K_t; L_t] = V_{12} Omega_t^-1``; and for *any* gains, the prediction and
filter errors are ``[I_2n, -[K; L]] z``, so

    [[P_{t+1|t}, .], [., P_{t|t}]] = M V M^T,   M = [I_2n, -[K; L]],

which is the Joseph form of both updates: ``(A - K C) P (A - K C)^T +
[G, -K H] Sigma [G, -K H]^T`` (the paper's (32) with ERRATA's
``K Omega K^T``) and ``(I - L C) P (I - L C)^T + L H R H^T L^T``; positive
semidefinite by construction, then symmetrised.

- Gains come from the Cholesky factor of ``Omega_t`` (for ``n_y = 1`` a
  division by the positive scalar); a factor that fails raises
  :class:`~lpvest.errors.NumericalError` naming ``t``. No inverse, no jitter.
- ``[E, [B; 0; D], W]`` is one matrix of degree two in the basis functions
  (``G Q G^T`` is quadratic); :class:`KalmanModel` packs its coefficients
  once, so a sample's matrices are one product ``z(p) @ coefficients``.
- One kernel (:func:`covariance_step`) serves the streaming filter, the
  sequential batch filter, the truncated filter and the fading-memory
  analysis.
- The batch filter :func:`kalman_filter` has a second algorithm, the
  parallel-in-time scan of Särkkä & García-Fernández (2021) on the
  decorrelated model (:mod:`lpvest.estimators.kalman_scan`): the same numbers
  from a few hundred batched numpy calls instead of ~14 small calls per
  sample; ``method="auto"`` chooses.

Runtime code: imports only numpy.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from ..errors import ArgumentError, ArgumentTypeError, DimensionError, NonFiniteError, NumericalError, abbreviate
from ..protocol import Port
from ..systems.affine import AffineLPV, NoiseCovariance
from ..validation import (
    as_matrix,
    as_rng,
    as_signal,
    as_vector,
    check_finite,
    check_positive_definite,
)
from .kalman_scan import (
    ScanAccuracyWarning,
    decorrelate_stack,
    scan_amplification,
    scan_error_bound,
    scan_filter,
)

__all__ = [
    "KalmanModel",
    "KalmanMatrices",
    "StepMatrices",
    "KalmanState",
    "CovarianceStep",
    "KalmanStep",
    "KalmanResult",
    "InnovationFormData",
    "covariance_step",
    "kalman_step",
    "kalman_filter",
    "simulate_innovation_form",
    "LPVKalmanFilter",
    "SCAN_MIN_SAMPLES",
    "SCAN_MAX_AMPLIFICATION",
    "ScanAccuracyWarning",
]

_LOG_2PI = math.log(2.0 * math.pi)


def _mT(x: np.ndarray) -> np.ndarray:
    """Transpose of the last two axes (works on stacks; numpy < 2 has no ``.mT``)."""
    return np.swapaxes(x, -1, -2)


# ---------------------------------------------------------------------------
# p-dependent matrices
# ---------------------------------------------------------------------------
class KalmanMatrices(NamedTuple):
    """The p-dependent matrices of (4c)-(4e) at one sample, or stacked along
    time (leading axis ``T``).

    ``GQG = G Q G^T`` (n_x, n_x), ``GSH = G S H^T`` (n_x, n_y),
    ``HRH = H R H^T`` (n_y, n_y); ``A, B, C, D`` as in (1).
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    GQG: np.ndarray
    GSH: np.ndarray
    HRH: np.ndarray


class StepMatrices(NamedTuple):
    """One sample's matrices (or a stack along time) in the layout of the
    recursion (module notes). With ``n = n_x``, ``m = n_y``::

        F = [[A, B, GQG, 0, GSH],
             [I, 0, 0,   0, 0  ],
             [C, D, GSH^T, 0, HRH]]     shape (2n + m, n + n_u + 2n + m)

    i.e. ``F = [E, [B; 0; D], W]``.
    """

    F: np.ndarray
    nx: int
    nu: int
    ny: int

    def readable(self) -> KalmanMatrices:
        """The same matrices as :class:`KalmanMatrices` (views)."""
        n, nu = self.nx, self.nu
        F, w = self.F, n + nu
        return KalmanMatrices(
            A=F[..., :n, :n],
            B=F[..., :n, n:w],
            C=F[..., 2 * n :, :n],
            D=F[..., 2 * n :, n:w],
            GQG=F[..., :n, w : w + n],
            GSH=F[..., :n, w + 2 * n :],
            HRH=F[..., 2 * n :, w + 2 * n :],
        )

    def at(self, t: int) -> StepMatrices:
        """Sample ``t`` of a stack."""
        return StepMatrices(self.F[t], self.nx, self.nu, self.ny)

    def window(self, start: int, stop: int) -> StepMatrices:
        """Samples ``start..stop-1`` of a stack."""
        return StepMatrices(self.F[start:stop], self.nx, self.nu, self.ny)


def _monomial_pairs(k: int) -> list[tuple[int, int]]:
    """Products ``psi_i psi_j`` (1 <= i <= j <= k) in the order of ``z``."""
    return [(i, j) for i in range(1, k + 1) for j in range(i, k + 1)]


@dataclass(frozen=True, eq=False)
class KalmanModel:
    """An :class:`~lpvest.systems.AffineLPV` compiled for the Kalman recursion.

    Every matrix the recursion needs is a polynomial of degree at most two in
    the basis functions ``psi_i(p)`` (``G Q G^T`` is quadratic), so it is one
    product ``z(p) @ coefficients`` with
    ``z = [1, psi_1, ..., psi_k, psi_i psi_j (i <= j)]``.

    Parameters
    ----------
    model : AffineLPV
    noise : NoiseCovariance or array_like, shape (n_w + n_v, n_w + n_v), optional
        The noise covariance the filter assumes (default: the model's), e.g.
        for tuning; a joint matrix ``[[Q, S], [S^T, R]]`` is checked to be
        positive definite.

    Examples
    --------
    >>> from lpvest import load_system
    >>> km = KalmanModel(load_system("cox-toth-truncation").model())
    >>> km.matrices([0.5]).GQG.shape
    (2, 2)
    """

    model: AffineLPV
    noise: NoiseCovariance

    def __init__(self, model: AffineLPV, *, noise: NoiseCovariance | object | None = None) -> None:
        if not isinstance(model, AffineLPV):
            raise ArgumentTypeError(f"the Kalman filter needs an AffineLPV model, not {type(model).__name__}")
        if noise is None:
            noise = model.noise
        elif not isinstance(noise, NoiseCovariance):
            nw, nv = model.nw, model.nv
            joint = as_matrix(noise, "noise covariance Sigma", (nw + nv, nw + nv))
            check_positive_definite(joint, "the joint noise covariance Sigma = [[Q, S], [S^T, R]]")
            noise = NoiseCovariance(joint[:nw, :nw], joint[nw:, nw:], joint[:nw, nw:])
        if noise.Q.shape != (model.nw, model.nw) or noise.R.shape != (model.nv, model.nv):
            raise DimensionError(
                f"noise has Q {noise.Q.shape}, R {noise.R.shape}; the model needs "
                f"({model.nw}, {model.nw}) and ({model.nv}, {model.nv})"
            )
        object.__setattr__(self, "model", model)
        object.__setattr__(self, "noise", noise)
        self._compile()

    # -- packing --------------------------------------------------------------
    def _compile(self) -> None:
        dep = self.model.dependence
        n, nu, m = self.model.nx, self.model.nu, self.model.ny
        k = len(dep.basis)
        pairs = _monomial_pairs(k)
        nz = 1 + k + len(pairs)
        co = {name: dep.coefficients[name] for name in ("A", "B", "C", "D", "G", "H")}
        Q, S, R = self.noise.Q, self.noise.S, self.noise.R

        def quad(left: np.ndarray, mid: np.ndarray, right: np.ndarray, sym: bool) -> np.ndarray:
            """Coefficients over z of (sum_i psi_i L_i) M (sum_j psi_j R_j)^T."""
            out = np.zeros((nz, left.shape[1], right.shape[1]))

            def term(i: int, j: int) -> np.ndarray:
                return left[i] @ mid @ right[j].T

            out[0] = term(0, 0)
            for i in range(1, k + 1):
                out[i] = term(0, i) + term(i, 0)
            for r, (i, j) in enumerate(pairs):
                out[1 + k + r] = term(i, j) if i == j else term(i, j) + term(j, i)
            if sym:
                out = 0.5 * (out + np.swapaxes(out, 1, 2))
            return out

        def lin(name: str) -> np.ndarray:
            out = np.zeros((nz, *co[name].shape[1:]))
            out[: k + 1] = co[name]
            return out

        A, B, C, D = lin("A"), lin("B"), lin("C"), lin("D")
        GQG = quad(co["G"], Q, co["G"], True)
        GSH = quad(co["G"], S, co["H"], False)
        HRH = quad(co["H"], R, co["H"], True)
        const = np.zeros(nz)
        const[0] = 1.0
        eye_n = const[:, None, None] * np.eye(n)

        def z(r: int, c: int) -> np.ndarray:
            return np.zeros((nz, r, c))

        def block(rows: list[list[np.ndarray]]) -> np.ndarray:
            return np.concatenate([np.concatenate(row, axis=2) for row in rows], axis=1)

        F = block(
            [
                [A, B, GQG, z(n, n), GSH],
                [eye_n, z(n, nu), z(n, n), z(n, n), z(n, m)],
                [C, D, np.swapaxes(GSH, 1, 2), z(m, n), HRH],
            ]
        )
        packed = F.reshape(nz, -1)
        plain = np.concatenate([M.reshape(nz, -1) for M in (A, B, C, D, GQG, GSH, HRH)], axis=1)
        plain_shapes = [M.shape[1:] for M in (A, B, C, D, GQG, GSH, HRH)]
        # the scan also wants A^T stored contiguously (see _scan_matrices_batch)
        scan = np.concatenate((plain, np.swapaxes(A, 1, 2).reshape(nz, -1)), axis=1)
        for arr in (packed, plain, scan):
            arr.setflags(write=False)
        basis = dep.basis
        from ..scheduling import Monomial

        monomial = all(isinstance(b, Monomial) for b in basis)
        # the common case psi_i(p) = p_j: read the components directly
        components = None
        if monomial and all(sorted(b.exponents) == [0] * (len(b.exponents) - 1) + [1] for b in basis):
            components = [b.exponents.index(1) for b in basis]
        space = self.model.space
        tol = 1e-12 * np.maximum(1.0, np.maximum(np.abs(space.lower), np.abs(space.upper)))
        object.__setattr__(
            self,
            "_c",
            {
                "packed": packed,
                "plain": plain,
                "plain_shapes": plain_shapes,
                "scan": scan,
                "shape": F.shape[1:],
                "pairs": pairs,
                "k": k,
                "basis": basis,
                "exponents": [b.exponents for b in basis] if monomial else None,
                "components": components,
                "lo": (space.lower - tol).tolist(),
                "hi": (space.upper + tol).tolist(),
            },
        )

    # -- dimensions -----------------------------------------------------------
    @property
    def nx(self) -> int:
        return self.model.nx

    @property
    def nu(self) -> int:
        return self.model.nu

    @property
    def ny(self) -> int:
        return self.model.ny

    @property
    def n_p(self) -> int:
        return self.model.n_p

    # -- evaluation -----------------------------------------------------------
    def check_p(self, p: np.ndarray, t: int | None = None) -> None:
        """Raise :class:`~lpvest.errors.SchedulingRangeError` if ``p`` (a finite
        float vector of the right length) lies outside the box."""
        c = self._c  # type: ignore[attr-defined]
        for v, lo, hi in zip(p.tolist(), c["lo"], c["hi"], strict=True):
            if v < lo or v > hi:
                what = "scheduling value" if t is None else f"scheduling value at t={t}:"
                self.model.space.check(p, what=what)  # raises with the standard message

    def z(self, p: np.ndarray) -> list[float]:
        """``z(p) = [1, psi_1, ..., psi_k, psi_i psi_j (i <= j)]``."""
        c = self._c  # type: ignore[attr-defined]
        comps = c["components"]
        exps = c["exponents"]
        if comps is not None:
            pl = p.tolist()
            psi = [pl[j] for j in comps]
        elif exps is not None:
            pl = p.tolist()
            psi = []
            for ex in exps:
                v = 1.0
                for pj, e in zip(pl, ex, strict=True):
                    if e:
                        v *= pj**e
                psi.append(v)
        else:
            psi = [b(p) for b in c["basis"]]
        return [1.0, *psi, *[psi[i - 1] * psi[j - 1] for i, j in c["pairs"]]]

    def z_batch(self, p: np.ndarray) -> np.ndarray:
        """``z`` along a trajectory ``p`` (T, n_p): shape (T, n_z)."""
        c = self._c  # type: ignore[attr-defined]
        T = p.shape[0]
        psi = np.empty((T, c["k"]))
        for i, b in enumerate(c["basis"]):
            psi[:, i] = b.evaluate(p)
        cols = [np.ones((T, 1)), psi] + [psi[:, i - 1 : i] * psi[:, j - 1 : j] for i, j in c["pairs"]]
        return np.concatenate(cols, axis=1)

    def step_matrices(self, p: object, *, check: bool = True) -> StepMatrices:
        """:class:`StepMatrices` at one scheduling vector ``p`` (n_p,)."""
        pv = as_vector(p, "p", self.n_p)
        if check:
            self.check_p(pv)
        return self._step_matrices(pv)

    def _step_matrices(self, p: np.ndarray) -> StepMatrices:
        c = self._c  # type: ignore[attr-defined]
        return StepMatrices(np.dot(self.z(p), c["packed"]).reshape(c["shape"]), self.nx, self.nu, self.ny)

    def step_matrices_batch(self, p: np.ndarray, *, check: bool = True) -> StepMatrices:
        """:class:`StepMatrices` stacked along a trajectory ``p`` (T, n_p)."""
        p = as_signal(p, "p", self.n_p)
        if check:
            self.check_box_batch(p)
        c = self._c  # type: ignore[attr-defined]
        F = (self.z_batch(p) @ c["packed"]).reshape(p.shape[0], *c["shape"])
        return StepMatrices(F, self.nx, self.nu, self.ny)

    def check_box_batch(self, p: np.ndarray) -> None:
        """Range-check a trajectory (T, n_p); the error names the first bad ``t``."""
        c = self._c  # type: ignore[attr-defined]
        bad = np.any((p < np.asarray(c["lo"])) | (p > np.asarray(c["hi"])), axis=1)
        if np.any(bad):
            t = int(np.argmax(bad))
            self.model.space.check(p[t], what=f"scheduling value at t={t}:")

    def matrices(self, p: object, *, check: bool = True) -> KalmanMatrices:
        """:class:`KalmanMatrices` at one scheduling vector ``p``."""
        pv = as_vector(p, "p", self.n_p)
        if check:
            self.check_p(pv)
        c = self._c  # type: ignore[attr-defined]
        flat = np.dot(self.z(pv), c["plain"])
        out, pos = [], 0
        for shp in c["plain_shapes"]:
            size = int(np.prod(shp))
            out.append(flat[pos : pos + size].reshape(shp))
            pos += size
        return KalmanMatrices(*out)

    def _scan_matrices_batch(self, p: np.ndarray) -> tuple[KalmanMatrices, np.ndarray]:
        """:class:`KalmanMatrices` along a checked trajectory and ``A^T``
        (T, n_x, n_x), every matrix contiguous, from one product."""
        c = self._c  # type: ignore[attr-defined]
        flat = self.z_batch(p) @ c["scan"]
        T = p.shape[0]
        out, pos = [], 0
        for shp in [*c["plain_shapes"], c["plain_shapes"][0]]:
            size = int(np.prod(shp))
            out.append(flat[:, pos : pos + size].reshape(T, *shp))
            pos += size
        return KalmanMatrices(*out[:-1]), out[-1]

    def matrices_batch(self, p: object, *, check: bool = True) -> KalmanMatrices:
        """:class:`KalmanMatrices` stacked along a trajectory ``p`` (T, n_p)."""
        p = as_signal(p, "p", self.n_p)
        if check:
            self.check_box_batch(p)
        c = self._c  # type: ignore[attr-defined]
        flat = self.z_batch(p) @ c["plain"]
        T = p.shape[0]
        out, pos = [], 0
        for shp in c["plain_shapes"]:
            size = int(np.prod(shp))
            out.append(flat[:, pos : pos + size].reshape(T, *shp))
            pos += size
        return KalmanMatrices(*out)


# ---------------------------------------------------------------------------
# the kernel
# ---------------------------------------------------------------------------
class CovarianceStep(NamedTuple):
    """What :func:`covariance_step` computes at one sample (or a stack)."""

    Omega: np.ndarray  #: (n_y, n_y) ``Omega_t``, (4e)
    gains: np.ndarray  #: (2 n_x, n_y) ``[K_t; L_t]``, (4c) and ERRATA (7)
    joint: np.ndarray  #: (2 n_x, 2 n_x) symmetric; blocks ``[:n, :n] = P_{t+1|t}``, ``[n:, n:] = P_{t|t}``
    whitened: np.ndarray | None  #: ``chol(Omega)^-1 rhs`` when ``rhs`` was given
    logdet: float | np.ndarray  #: ``log det Omega_t``


def _singular(t: int | None, detail: str) -> NumericalError:
    where = "" if t is None else f" at t={t}"
    return NumericalError(f"the innovation covariance Omega_t is not positive definite{where}: {detail}")


_EYE: dict[int, np.ndarray] = {}


def _eye(k: int) -> np.ndarray:
    e = _EYE.get(k)
    if e is None:
        e = np.eye(k)
        e.setflags(write=False)
        _EYE[k] = e
    return e


_SMALL = 3  #: largest n_y handled by :func:`_small_chol_inverse`


def _small_chol_inverse(Omega: np.ndarray, t: int | None) -> tuple[np.ndarray, float]:
    """``chol^-1`` and ``log det`` of a small symmetric positive definite
    matrix: the Cholesky factor by the textbook recurrence, its inverse by
    forward substitution on the identity, in Python floats."""
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
                if not 0.0 < s < math.inf:
                    raise _singular(t, f"Cholesky pivot {i + 1} is {s:.3g}")
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


def covariance_step(
    P: np.ndarray,
    sm: StepMatrices,
    *,
    t: int | None = None,
    gains: np.ndarray | None = None,
    rhs: np.ndarray | None = None,
) -> CovarianceStep:
    """Gains and Joseph-form covariances from ``P_{t|t-1}``; pure.

    ``V = E P E^T + W`` (module notes) gives ``Omega_t`` (4e) and the optimal
    gains ``[K_t; L_t] = V_12 Omega_t^-1`` ((4c), ERRATA (7)), by Cholesky
    solves; ``M V M^T`` with ``M = [I, -[K; L]]`` gives ``P_{t+1|t}`` and
    ``P_{t|t}`` in Joseph form ((32) with ERRATA), symmetrised. The Joseph
    forms hold for any gains, so ``gains`` may be given (a suboptimal filter):
    the covariances are then the true error covariances of that filter.

    Parameters
    ----------
    P : ndarray, shape (n_x, n_x) or (N, n_x, n_x)
        ``P_{t|t-1}`` (one, or a stack).
    sm : StepMatrices
        Matrices at ``p_t``, stacked like ``P``.
    t : int, optional
        Time index, named in errors.
    gains : ndarray, shape (2 n_x, n_y) or (N, 2 n_x, n_y), optional
        ``[K; L]`` to use instead of the optimal ones.
    rhs : ndarray, shape (n_y,), optional
        A vector to whiten, ``chol(Omega)^-1 rhs`` (one solve shared with
        the gains); unstacked use only.

    Raises
    ------
    NumericalError
        ``Omega_t`` is not positive definite (singular, or non-finite).

    Examples
    --------
    >>> from lpvest import load_system
    >>> km = KalmanModel(load_system("cox-toth-truncation").model())
    >>> cs = covariance_step(np.eye(2), km.step_matrices([0.3]))
    >>> cs.gains.shape, cs.joint.shape
    ((4, 2), (4, 4))
    """
    if P.ndim > 2:
        return _covariance_step_stack(P, sm, t, gains)
    n, m = sm.nx, sm.ny
    F = sm.F
    n2 = 2 * n
    E = F[:, :n]
    V = E @ P @ E.T
    V += F[:, n + sm.nu :]
    whitened = None
    if m == 1:
        w = float(V[n2, n2])
        if not 0.0 < w < math.inf:
            raise _singular(t, f"Omega_t = {w:.6g}")
        if gains is None:
            gains = V[:n2, n2:] / w
        if rhs is not None:
            whitened = rhs / math.sqrt(w)
        logdet = math.log(w)
    elif m <= _SMALL:
        # tiny Omega: its Cholesky factor and the factor's inverse (forward
        # substitution on I) in Python floats beat two LAPACK calls
        Ci, logdet = _small_chol_inverse(V[n2:, n2:], t)
        if gains is None:
            Z = Ci @ V[n2:, :n2]  # chol^-1 V_21
            gains = Z.T @ Ci  # V_12 chol^-T chol^-1 = V_12 Omega^-1
        if rhs is not None:
            whitened = Ci @ rhs
    else:
        Omega = V[n2:, n2:]
        try:
            chol = np.linalg.cholesky(Omega)
        except np.linalg.LinAlgError as exc:
            raise _singular(t, f"smallest eigenvalue {np.linalg.eigvalsh(Omega)[0]:.3g}") from exc
        if not np.all(np.isfinite(chol)):
            raise _singular(t, "it holds non-finite values")
        logdet = 2.0 * float(np.sum(np.log(np.diagonal(chol))))
        if gains is None:
            # one forward substitution: chol^-1 [V_21, I, rhs]; then
            # [K; L] = V_12 chol^-T chol^-1 = (chol^-1 V_21)^T chol^-1
            parts = [V[n2:, :n2], _eye(m)]
            if rhs is not None:
                parts.append(rhs[:, None])
            Z = np.linalg.solve(chol, np.concatenate(parts, axis=1))
            gains = Z[:, :n2].T @ Z[:, n2 : n2 + m]
            if rhs is not None:
                whitened = Z[:, -1]
        elif rhs is not None:
            whitened = np.linalg.solve(chol, rhs)
    M = np.concatenate((_eye(n2), -gains), axis=1)
    PP = M @ V @ M.T
    PP = PP + PP.T
    PP *= 0.5
    return CovarianceStep(V[n2:, n2:], gains, PP, whitened, logdet)


def _covariance_step_stack(
    P: np.ndarray, sm: StepMatrices, t: int | None, gains: np.ndarray | None
) -> CovarianceStep:
    n = sm.nx
    n2 = 2 * n
    F = sm.F
    E = F[..., :n]
    V = E @ P @ _mT(E) + F[..., n + sm.nu :]
    Omega = V[..., n2:, n2:]
    try:
        chol = np.linalg.cholesky(Omega)
    except np.linalg.LinAlgError as exc:
        bad = np.linalg.eigvalsh(Omega)[..., 0] <= 0
        raise _singular(t, f"in stack element {int(np.argmax(bad.reshape(-1)))}") from exc
    if not np.all(np.isfinite(chol)):
        raise _singular(t, "it holds non-finite values")
    if gains is None:
        gains = _mT(np.linalg.solve(_mT(chol), np.linalg.solve(chol, V[..., n2:, :n2])))
    M = np.concatenate((np.broadcast_to(_eye(n2), (*gains.shape[:-2], n2, n2)), -gains), axis=-1)
    PP = M @ V @ _mT(M)
    logdet = 2.0 * np.sum(np.log(np.diagonal(chol, axis1=-2, axis2=-1)), axis=-1)
    return CovarianceStep(Omega, gains, 0.5 * (PP + _mT(PP)), None, logdet)


# ---------------------------------------------------------------------------
# one sample
# ---------------------------------------------------------------------------
class KalmanState(NamedTuple):
    """The predictor's state before sample ``t``: ``x^_{t|t-1}``, ``P_{t|t-1}``."""

    x: np.ndarray  #: (n_x,)
    P: np.ndarray  #: (n_x, n_x)
    t: int = 0


class KalmanStep(NamedTuple):
    """Everything the filter computes from sample ``t``."""

    t: int
    y_pred: np.ndarray  #: (n_y,) ``C x^_{t|t-1} + D u_t``
    innovation: np.ndarray  #: (n_y,) ``xi_t``, (4b)
    Omega: np.ndarray  #: (n_y, n_y) ``Omega_t``, (4e)
    K: np.ndarray  #: (n_x, n_y) predictor gain ``K_t``, (4c)
    L: np.ndarray  #: (n_x, n_y) filter gain ``L_t = P C^T Omega^-1``
    x_filt: np.ndarray  #: (n_x,) ``x^_{t|t}``
    P_filt: np.ndarray  #: (n_x, n_x) ``P_{t|t}``
    next: KalmanState  #: ``x^_{t+1|t}``, ``P_{t+1|t}`` ((4a), (4d)), ``t + 1``
    log_likelihood: float  #: ``log N(y_t; y_pred, Omega_t)``


def kalman_step(
    state: KalmanState,
    sm: StepMatrices,
    u: np.ndarray,
    y: np.ndarray,
    *,
    gains: np.ndarray | None = None,
) -> KalmanStep:
    """One sample of (4a)-(4e) plus the filtered estimate; pure.

    Parameters
    ----------
    state : KalmanState
        ``x^_{t|t-1}``, ``P_{t|t-1}``, ``t``.
    sm : StepMatrices
        Matrices at ``p_t`` (:meth:`KalmanModel.step_matrices`).
    u : ndarray, shape (n_u,)
    y : ndarray, shape (n_y,)
    gains : ndarray, shape (2 n_x, n_y), optional
        ``[K; L]`` to use instead of the optimal gains from ``state.P``.

    Returns
    -------
    KalmanStep

    Examples
    --------
    >>> from lpvest import load_system
    >>> km = KalmanModel(load_system("cox-toth-truncation").model())
    >>> s0 = KalmanState(km.model.x0, km.model.P0)
    >>> out = kalman_step(s0, km.step_matrices([0.0]), np.zeros(1), np.array([0.1, -0.2]))
    >>> out.next.t, out.K.shape
    (1, (2, 2))
    """
    n, nu, m = sm.nx, sm.nu, sm.ny
    F = sm.F
    if nu:
        h = F[:, : n + nu] @ np.concatenate((state.x, u))  # [A x + B u; x; C x + D u]
    else:
        h = F[:, :n] @ state.x
    n2 = 2 * n
    y_pred = h[n2:]
    xi = y - y_pred
    cs = covariance_step(state.P, sm, t=state.t, gains=gains, rhs=xi)
    G = cs.gains
    xs = h[:n2] + G @ xi  # [x^_{t+1|t}; x^_{t|t}]
    z = cs.whitened
    assert z is not None
    ll = -0.5 * (m * _LOG_2PI + cs.logdet + float(z @ z))
    PP = cs.joint
    return KalmanStep(
        t=state.t,
        y_pred=y_pred,
        innovation=xi,
        Omega=cs.Omega,
        K=G[:n],
        L=G[n:],
        x_filt=xs[n:],
        P_filt=PP[n:, n:],
        next=KalmanState(xs[:n], PP[:n, :n], state.t + 1),
        log_likelihood=ll,
    )


# ---------------------------------------------------------------------------
# whole trajectories
# ---------------------------------------------------------------------------
class KalmanResult(NamedTuple):
    """The exact filter over a trajectory of ``T`` samples; row ``t`` is time ``t``."""

    predicted_means: np.ndarray  #: (T + 1, n_x) ``x^_{t|t-1}``, t = 0..T
    predicted_covariances: np.ndarray  #: (T + 1, n_x, n_x) ``P_{t|t-1}``
    filtered_means: np.ndarray  #: (T, n_x) ``x^_{t|t}``
    filtered_covariances: np.ndarray  #: (T, n_x, n_x) ``P_{t|t}``
    predicted_outputs: np.ndarray  #: (T, n_y) ``C x^_{t|t-1} + D u_t``
    innovations: np.ndarray  #: (T, n_y) ``xi_t``
    innovation_covariances: np.ndarray  #: (T, n_y, n_y) ``Omega_t``
    gains: np.ndarray  #: (T, n_x, n_y) ``K_t``
    filter_gains: np.ndarray  #: (T, n_x, n_y) ``L_t``
    log_likelihood_terms: np.ndarray  #: (T,) ``log N(y_t; y^_t, Omega_t)``
    log_likelihood: float  #: ``log p(y_0, ..., y_{T-1})``


def _initial(km: KalmanModel, x0: object | None, P0: object | None) -> tuple[np.ndarray, np.ndarray]:
    n = km.nx
    x = km.model.x0.copy() if x0 is None else as_vector(x0, "x0", n)
    if P0 is None:
        P = km.model.P0.copy()
    else:
        P = check_positive_definite(as_matrix(P0, "P0", (n, n)), "P0", semidefinite=True).copy()
    return x, P


def _riccati_sweep(
    km: KalmanModel, sms: StepMatrices, P0: np.ndarray, *, t0: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The covariance recursion alone along stacked matrices (the only part
    of the filter that must run sample by sample): returns ``P_{t|t-1}``
    (T + 1), ``P_{t|t}`` (T), ``Omega_t`` (T), ``[K_t; L_t]`` (T)."""
    T = sms.F.shape[0]
    n, nu, m = km.nx, km.nu, km.ny
    Pp = np.empty((T + 1, n, n))
    Pf = np.empty((T, n, n))
    Om = np.empty((T, m, m))
    Gm = np.empty((T, 2 * n, m))
    P = P0
    Pp[0] = P
    step = covariance_step
    for t, F in enumerate(sms.F):
        cs = step(P, StepMatrices(F, n, nu, m), t=t0 + t)
        PP = cs.joint
        P = PP[:n, :n]
        Pp[t + 1] = P
        Pf[t] = PP[n:, n:]
        Om[t] = cs.Omega
        Gm[t] = cs.gains
    return Pp, Pf, Om, Gm


#: ``kalman_filter(method="auto")`` runs the sequential recursion for fewer
#: samples than this: the scan's fixed cost of a few hundred numpy calls is
#: then not recovered (measured with ``benchmarks/bench_kalman.py``: with
#: blocks of at least :data:`~lpvest.estimators.kalman_scan.MIN_BLOCK`
#: samples, for accuracy, the two break even between 64 and 96 samples for
#: n_x = 2 and 10: 1.5 / 1.7 ms at 64, 2.0 / 1.7 ms at 96).
#: There is no rule on n_x: per sample the scan does fewer flops than the
#: sequential kernel, and it was faster at every n_x measured (2 to 100).
SCAN_MIN_SAMPLES = 80

#: ``kalman_filter(method="auto")`` runs the sequential recursion when
#: ``amp = max_t ||J_t||_F ||C_t||_F`` (a bound of ``||J_t C_t||_F``) exceeds
#: this, ``J_t = G S H^T (H R H^T)^-1``: the decorrelated form amplifies
#: rounding errors by about ``amp^2`` (a nearly singular ``H R H^T`` next to
#: a strong cross-covariance), see :mod:`lpvest.estimators.kalman_scan`,
#: "Accuracy". Up to this gate the scan's own part of its documented accuracy
#: (:func:`~lpvest.estimators.kalman_scan.scan_error_bound`,
#: ``100 eps (kappa + (1 + amp)^2)`` with ``kappa = max_t cond(Omega_t)``
#: the part any algorithm shares) is at most ``100 eps 31^2 = 2.1e-11``
#: relative to each output's size; beyond it, ``method="scan"`` runs but
#: warns (:class:`ScanAccuracyWarning`).
SCAN_MAX_AMPLIFICATION = 30.0

_METHODS = ("auto", "scan", "sequential")


def kalman_filter(
    model: AffineLPV | KalmanModel,
    p: object,
    u: object | None,
    y: object,
    *,
    x0: object | None = None,
    P0: object | None = None,
    noise: NoiseCovariance | object | None = None,
    method: str = "auto",
) -> KalmanResult:
    """Run the exact filter (4a)-(4e) over a whole trajectory.

    The matrices for every sample are evaluated at once. Two algorithms give
    the same numbers to rounding: the scan's outputs are within
    :func:`~lpvest.estimators.kalman_scan.scan_error_bound` of the
    sequential recursion's (``100 eps (kappa + (1 + amp)^2)`` relative to
    each output's largest entry, ``kappa = max_t cond(Omega_t)``; the scan's
    own part is at most 2.1e-11 where ``"auto"`` takes it), and the tests
    hold both to a Gaussian-conditioning oracle within about
    ``50 eps cond(S_yy)`` plus that bound:

    - ``"sequential"``: the covariance recursion (:func:`covariance_step`,
      the streaming filter's kernel) runs sample by sample; means, filtered
      estimates and the log-likelihood follow for all samples together.
    - ``"scan"``: the parallel-in-time filter of Särkkä & García-Fernández
      (2021) on the decorrelated model, as a blocked associative scan of
      batched small-matrix operations
      (:mod:`lpvest.estimators.kalman_scan`). It needs ``H R H^T`` positive
      definite at every sample (raises :class:`~lpvest.errors.NumericalError`
      naming the first ``t`` where it is not). Where the error
      amplification ``amp = max_t ||J_t||_F ||C_t||_F`` is above
      :data:`SCAN_MAX_AMPLIFICATION` it still runs, but warns
      (:class:`ScanAccuracyWarning`, with the error bound).
    - ``"auto"`` (default): the scan, except when it does not apply or does
      not pay: ``H R H^T`` singular at some sample, fewer than
      :data:`SCAN_MIN_SAMPLES` samples, or ``amp`` above
      :data:`SCAN_MAX_AMPLIFICATION` (module notes of
      :mod:`~lpvest.estimators.kalman_scan`); then the sequential
      recursion. (An empty trajectory has nothing to scan: every method
      returns the initial prediction.)

    Parameters
    ----------
    model : AffineLPV or KalmanModel
    p : array_like, shape (T, n_p)
        Scheduling trajectory (range-checked).
    u : array_like, shape (T, n_u), or None when n_u = 0
    y : array_like, shape (T, n_y)
    x0, P0 : array_like, optional
        Initial mean and covariance (default: the model's). ``P0`` may be
        singular.
    noise : NoiseCovariance or array_like, optional
        The noise covariance to assume (default: the model's).
    method : {"auto", "scan", "sequential"}
        The algorithm (above).

    Returns
    -------
    KalmanResult

    Raises
    ------
    DimensionError, NonFiniteError, SchedulingRangeError, NotPositiveDefiniteError
        Bad input.
    NumericalError
        ``Omega_t`` is singular, or (``method="scan"``) ``H R H^T`` is; the
        message names ``t``.
    ArgumentError, ArgumentTypeError
        ``method`` is not one of the three names (they derive from
        ``ValueError`` and ``TypeError``).

    Warns
    -----
    ScanAccuracyWarning
        ``method="scan"`` where ``amp > SCAN_MAX_AMPLIFICATION``.

    Examples
    --------
    >>> from lpvest import load_system
    >>> model = load_system("cox-toth-truncation").model()
    >>> k = np.arange(200)
    >>> p = np.sin(0.25 * k)[:, None]
    >>> u = np.sin(0.1 * k)[:, None]
    >>> data = model.simulate(p, u, rng=0)
    >>> res = kalman_filter(model, p, u, data.y)
    >>> res.gains.shape, res.predicted_means.shape
    ((200, 2, 2), (201, 2))
    >>> seq = kalman_filter(model, p, u, data.y, method="sequential")
    >>> err = np.max(np.abs(res.predicted_covariances - seq.predicted_covariances))
    >>> bool(err < 1e-12 * np.max(np.abs(seq.predicted_covariances)))
    True
    """
    if not isinstance(method, str):
        raise ArgumentTypeError(f"method must be a string, one of {', '.join(map(repr, _METHODS))}; "
                                f"found {abbreviate(method, 30)}")
    if method not in _METHODS:
        raise ArgumentError(f"method must be one of {', '.join(map(repr, _METHODS))}; found {abbreviate(method, 30)}")
    km = model if isinstance(model, KalmanModel) and noise is None else KalmanModel(
        model.model if isinstance(model, KalmanModel) else model, noise=noise
    )
    p = as_signal(p, "p", km.n_p)
    T = p.shape[0]
    u = as_signal(u, "u", km.nu, T)
    y = as_signal(y, "y", km.ny, T)
    x, P = _initial(km, x0, P0)
    km.check_box_batch(p)
    if method == "scan" or (method == "auto" and T >= SCAN_MIN_SAMPLES):
        # the scan wants each matrix contiguous (the sequential kernel, one packed F)
        mats, AT = km._scan_matrices_batch(p)
        res = _kalman_filter_scan(mats, AT, u, y, x, P, strict=method == "scan")
        if res is not None:
            return res
    sms = km.step_matrices_batch(p, check=False)
    return _kalman_filter_sequential(km, sms, sms.readable(), u, y, x, P)


def _kalman_filter_sequential(
    km: KalmanModel, sms: StepMatrices, mats: KalmanMatrices, u: np.ndarray, y: np.ndarray,
    x: np.ndarray, P: np.ndarray,
) -> KalmanResult:
    n, nu, m = km.nx, km.nu, km.ny
    T = y.shape[0]
    Pp, Pf, Om, Gm = _riccati_sweep(km, sms, P)
    K = Gm[:, :n]
    L = Gm[:, n:]
    # means: x_{t+1} = (A - K C) x_t + B u + K (y - D u), one matrix-vector product per step
    Du = np.einsum("tij,tj->ti", mats.D, u) if nu else np.zeros((T, m))
    c = np.einsum("tij,tj->ti", K, y - Du)
    if nu:
        c += np.einsum("tij,tj->ti", mats.B, u)
    xs = [x]
    for Ft, ct in zip(mats.A - K @ mats.C, c, strict=True):
        x = Ft @ x
        x += ct
        xs.append(x)
    xp = np.array(xs)
    y_pred = np.einsum("tij,tj->ti", mats.C, xp[:T]) + Du
    xi = y - y_pred
    xf = xp[:T] + np.einsum("tij,tj->ti", L, xi)
    return _result(xp, Pp, xf, Pf, y_pred, xi, Om, K, L)


def _kalman_filter_scan(
    mats: KalmanMatrices, AT: np.ndarray, u: np.ndarray, y: np.ndarray, x: np.ndarray, P: np.ndarray,
    *, strict: bool,
) -> KalmanResult | None:
    """The scan (:mod:`.kalman_scan`); ``None`` when ``strict`` is false and
    the scan does not apply (``H R H^T`` singular somewhere, or the error
    amplification is above :data:`SCAN_MAX_AMPLIFICATION`). With ``strict``
    (``method="scan"``) an amplification above the gate warns
    (:class:`ScanAccuracyWarning`) and the scan runs."""
    T = y.shape[0]
    if T == 0:
        return None
    dec = decorrelate_stack(*mats, u, y, AT=AT)
    if isinstance(dec, int):
        if not strict:
            return None
        raise NumericalError(
            f"method='scan' needs H(p) R H(p)^T positive definite (the decorrelation "
            f"J = G S H^T (H R H^T)^-1); it is not at t={dec}: use method='sequential' or 'auto'"
        )
    amp = scan_amplification(dec, mats.C)
    if amp > SCAN_MAX_AMPLIFICATION:
        if not strict:
            return None
        warnings.warn(
            f"method='scan': the decorrelation amplifies rounding errors by about amp^2 with "
            f"amp = max_t ||J_t|| ||C_t|| = {amp:.3g} > {SCAN_MAX_AMPLIFICATION:g} (SCAN_MAX_AMPLIFICATION; "
            f"H R H^T is small next to the cross-covariance G S H^T): the results may differ from the "
            f"sequential recursion by up to ~{scan_error_bound(amp):.1g} relative; method='auto' or "
            f"'sequential' runs the sequential recursion",
            ScanAccuracyWarning,
            stacklevel=3,
        )
    s = scan_filter(dec, mats.C, mats.HRH, x, P)
    return KalmanResult(
        predicted_means=s.xp,
        predicted_covariances=s.Pp,
        filtered_means=s.xf,
        filtered_covariances=s.Pf,
        predicted_outputs=y - s.xi,
        innovations=s.xi,
        innovation_covariances=s.Omega,
        gains=s.K,
        filter_gains=s.L,
        log_likelihood_terms=s.log_likelihood_terms,
        log_likelihood=float(np.sum(s.log_likelihood_terms)),
    )


def _result(
    xp: np.ndarray, Pp: np.ndarray, xf: np.ndarray, Pf: np.ndarray, y_pred: np.ndarray, xi: np.ndarray,
    Om: np.ndarray, K: np.ndarray, L: np.ndarray,
) -> KalmanResult:
    terms = _loglik_terms(xi, Om)
    return KalmanResult(
        predicted_means=xp,
        predicted_covariances=Pp,
        filtered_means=xf,
        filtered_covariances=Pf,
        predicted_outputs=y_pred,
        innovations=xi,
        innovation_covariances=Om,
        gains=K,
        filter_gains=L,
        log_likelihood_terms=terms,
        log_likelihood=float(np.sum(terms)),
    )


def _loglik_terms(xi: np.ndarray, Omega: np.ndarray) -> np.ndarray:
    """``log N(xi_t; 0, Omega_t)`` for all t, by Cholesky factors."""
    m = xi.shape[1]
    if m == 1:
        w = Omega[:, 0, 0]
        return -0.5 * (_LOG_2PI + np.log(w) + xi[:, 0] ** 2 / w)
    chol = np.linalg.cholesky(Omega)
    z = np.linalg.solve(chol, xi[..., None])[..., 0]
    logdet = 2.0 * np.sum(np.log(np.diagonal(chol, axis1=1, axis2=2)), axis=1)
    return -0.5 * (m * _LOG_2PI + logdet + np.sum(z * z, axis=1))


# ---------------------------------------------------------------------------
# innovation-form simulator
# ---------------------------------------------------------------------------
class InnovationFormData(NamedTuple):
    """Data generated from the innovation form (4); row ``t`` is time ``t``."""

    x: np.ndarray  #: (T, n_x) the innovation-form state ``x^_t`` of (4a)
    y: np.ndarray  #: (T, n_y)
    innovations: np.ndarray  #: (T, n_y) ``xi_t ~ N(0, Omega_t)``
    gains: np.ndarray  #: (T, n_x, n_y) ``K_t``
    innovation_covariances: np.ndarray  #: (T, n_y, n_y) ``Omega_t``


def simulate_innovation_form(
    model: AffineLPV | KalmanModel,
    p: object,
    u: object | None = None,
    *,
    rng: np.random.Generator | int | None = None,
    x0: object | None = None,
    P0: object | None = None,
) -> InnovationFormData:
    """Generate data from the innovation form (4a)-(4b).

    ``K_t`` and ``Omega_t`` come from the Riccati recursion (4c)-(4e) started
    at ``P0``; ``xi_t ~ N(0, Omega_t)`` independent; the state starts at
    ``x0``. The output has the same distribution as the general-noise model
    (1) with ``x_0 ~ N(x0, P0)`` (Lemma 1).

    Parameters
    ----------
    model : AffineLPV or KalmanModel
    p : array_like, shape (T, n_p)
    u : array_like, shape (T, n_u), optional (zero when omitted)
    rng : numpy.random.Generator or int, optional
        Random source or seed.
    x0, P0 : array_like, optional
        Initial mean and covariance (default: the model's).

    Examples
    --------
    >>> from lpvest import load_system
    >>> model = load_system("cox-toth-truncation").model()
    >>> data = simulate_innovation_form(model, np.zeros((50, 1)), np.ones((50, 1)), rng=1)
    >>> data.y.shape
    (50, 2)
    """
    km = model if isinstance(model, KalmanModel) else KalmanModel(model)
    n, nu, m = km.nx, km.nu, km.ny
    p = as_signal(p, "p", km.n_p)
    T = p.shape[0]
    u = as_signal(u if u is not None else np.zeros((T, nu)), "u", nu, T)
    x, P = _initial(km, x0, P0)
    sms = km.step_matrices_batch(p)
    _, _, Om, Gm = _riccati_sweep(km, sms, P)
    K = Gm[:, :n]
    xi = np.einsum("tij,tj->ti", np.linalg.cholesky(Om), as_rng(rng).standard_normal((T, m)))
    mats = sms.readable()
    X = np.empty((T, n))
    Y = np.empty((T, m))
    for t in range(T):
        X[t] = x
        Y[t] = mats.C[t] @ x + mats.D[t] @ u[t] + xi[t]
        x = mats.A[t] @ x + mats.B[t] @ u[t] + K[t] @ xi[t]
    return InnovationFormData(X, Y, xi, K, Om)


# ---------------------------------------------------------------------------
# streaming
# ---------------------------------------------------------------------------
class _Reader:
    """Fast validation of one sample's inputs (p, u, y) for a streaming filter."""

    def __init__(self, km: KalmanModel) -> None:
        self.km = km
        self.names = ("p", "u", "y") if km.nu else ("p", "y")
        self.sizes = {"p": km.n_p, "u": km.nu, "y": km.ny}
        self._nu = km.nu
        self._keys = frozenset(self.names)

    def _vec(self, inputs: Mapping[str, Any], name: str) -> np.ndarray:
        try:
            value = inputs[name]
        except KeyError:
            raise DimensionError(
                f"input {name!r} is missing; the inputs are {', '.join(self.names)}"
            ) from None
        try:
            a = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            a = None
        n = self.sizes[name]
        if a is None or a.shape != (n,):
            a = as_vector(value, name, n)
        return a

    def read(self, inputs: Mapping[str, Any], t: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if len(inputs) != len(self.names) or not self._keys.issuperset(inputs):
            extra = sorted(set(inputs) - self._keys)
            if extra:
                raise DimensionError(f"unknown input {abbreviate(extra[0], 30)}; the inputs are "
                                     f"{', '.join(self.names)}")
        p = self._vec(inputs, "p")
        y = self._vec(inputs, "y")
        u = self._vec(inputs, "u") if self._nu else _EMPTY
        total = sum(p.tolist()) + sum(y.tolist()) + (sum(u.tolist()) if self._nu else 0.0)
        if not math.isfinite(total):  # NaN/inf somewhere (or an overflowing sum)
            for name, arr in (("p", p), ("u", u), ("y", y)):
                check_finite(arr, f"{name} at t={t}")
        self.km.check_p(p, t)
        return p, u, y


_EMPTY = np.zeros(0)
_EMPTY.setflags(write=False)


def _ports_in(km: KalmanModel) -> tuple[Port, ...]:
    ports = [Port("p", (km.n_p,), "scheduling p_t")]
    if km.nu:
        ports.append(Port("u", (km.nu,), "input u_t"))
    ports.append(Port("y", (km.ny,), "measurement y_t"))
    return tuple(ports)


class LPVKalmanFilter:
    """The exact LPV Kalman filter (4a)-(4e) as a streaming estimator.

    Follows the streaming protocol (:mod:`lpvest.protocol`).

    Inputs (per sample ``t``): ``p`` (n_p,), ``u`` (n_u,) only if n_u > 0,
    ``y`` (n_y,).

    Outputs: ``xhat`` (n_x,) filtered ``x^_{t|t}``; ``P`` (n_x, n_x) its
    covariance ``P_{t|t}``; ``xpred`` (n_x,) ``x^_{t+1|t}``; ``Ppred``
    (n_x, n_x) ``P_{t+1|t}``; ``yhat`` (n_y,) ``C x^_{t|t-1} + D u_t``;
    ``innovation`` (n_y,) ``xi_t``; ``K`` (n_x, n_y) ``K_t``; ``Omega``
    (n_y, n_y) ``Omega_t``; ``loglik`` (scalar) ``log p(y_0, ..., y_t)``, the
    log-likelihood of the samples up to and including this one.

    Parameters
    ----------
    model : AffineLPV
    x0, P0 : array_like, optional
        Initial mean and covariance of ``x_0`` (default: the model's ``x0``,
        ``P0``).
    noise : NoiseCovariance or array_like, optional
        The noise covariance the filter assumes (default: the model's).

    Examples
    --------
    >>> from lpvest import load_system
    >>> kf = LPVKalmanFilter(load_system("cox-toth-truncation").model())
    >>> out = kf.step({"p": [0.0], "u": [1.0], "y": [0.1, -0.2]})
    >>> out["xhat"].shape, kf.t
    ((2,), 1)
    """

    def __init__(
        self,
        model: AffineLPV,
        *,
        x0: object | None = None,
        P0: object | None = None,
        noise: NoiseCovariance | object | None = None,
    ) -> None:
        self._km = KalmanModel(model, noise=noise)
        self._x0, self._P0 = _initial(self._km, x0, P0)
        self._x0.setflags(write=False)
        self._P0.setflags(write=False)
        self._reader = _Reader(self._km)
        n, m = self._km.nx, self._km.ny
        self._in = _ports_in(self._km)
        self._out = (
            Port("xhat", (n,), "filtered state x_{t|t}"),
            Port("P", (n, n), "covariance P_{t|t} of xhat"),
            Port("xpred", (n,), "predicted state x_{t+1|t}"),
            Port("Ppred", (n, n), "covariance P_{t+1|t} of xpred"),
            Port("yhat", (m,), "one-step output prediction C x_{t|t-1} + D u_t"),
            Port("innovation", (m,), "innovation xi_t = y_t - yhat"),
            Port("K", (n, m), "predictor gain K_t (4c)"),
            Port("Omega", (m, m), "innovation covariance Omega_t (4e)"),
            Port("loglik", (), "log-likelihood log p(y_0..y_t) of the samples up to this one"),
        )
        self.reset()

    # -- protocol ---------------------------------------------------------------
    @property
    def input_ports(self) -> tuple[Port, ...]:
        return self._in

    @property
    def output_ports(self) -> tuple[Port, ...]:
        return self._out

    @property
    def kalman_model(self) -> KalmanModel:
        return self._km

    def reset(self) -> None:
        """Back to ``x^_{0|-1} = x0``, ``P_{0|-1} = P0``, ``t = 0``."""
        self._state = KalmanState(self._x0, self._P0, 0)
        self._loglik = 0.0
        self._pending: tuple[bytes, KalmanStep] | None = None

    @property
    def state(self) -> KalmanState:
        """``x^_{t|t-1}``, ``P_{t|t-1}`` and ``t`` of the next sample."""
        return self._state

    @property
    def t(self) -> int:
        return self._state.t

    @property
    def log_likelihood(self) -> float:
        """``log p(y_0, ..., y_{t-1})`` of the samples consumed so far."""
        return self._loglik

    def _compute(self, inputs: Mapping[str, Any], keep: bool = False) -> tuple[bytes, KalmanStep]:
        st = self._state
        p, u, y = self._reader.read(inputs, st.t)
        pend = self._pending
        key = b""
        if keep or pend is not None:  # outputs() then step() on the same sample: compute once
            key = p.tobytes() + u.tobytes() + y.tobytes()
            if pend is not None and pend[0] == key and pend[1].t == st.t:
                return pend
        return key, kalman_step(st, self._km._step_matrices(p), u, y)

    def process(self, p: object, u: object | None, y: object) -> KalmanStep:
        """Consume sample ``t`` and advance; returns every quantity of the step
        (``K_t``, ``Omega_t``, ``L_t``, ...)."""
        inputs = {"p": p, "y": y} if not self._km.nu else {"p": p, "u": u, "y": y}
        return self._advance(self._compute(inputs)[1])

    def peek(self, p: object, u: object | None, y: object) -> KalmanStep:
        """Like :meth:`process` without changing the filter."""
        inputs = {"p": p, "y": y} if not self._km.nu else {"p": p, "u": u, "y": y}
        return self._compute(inputs)[1]

    def _advance(self, res: KalmanStep) -> KalmanStep:
        nxt = res.next
        nxt.x.setflags(write=False)
        nxt.P.setflags(write=False)
        self._state = nxt
        self._loglik += res.log_likelihood
        self._pending = None
        return res

    @staticmethod
    def _as_dict(r: KalmanStep, loglik: float) -> dict[str, np.ndarray]:
        return {
            "xhat": r.x_filt,
            "P": r.P_filt,
            "xpred": r.next.x,
            "Ppred": r.next.P,
            "yhat": r.y_pred,
            "innovation": r.innovation,
            "K": r.K,
            "Omega": r.Omega,
            "loglik": np.array(loglik + r.log_likelihood),
        }

    def outputs(self, inputs: Mapping[str, Any]) -> dict[str, np.ndarray]:
        """Estimates at the current sample; no state change."""
        key, res = self._compute(inputs, keep=True)
        self._pending = (key, res)
        return self._as_dict(res, self._loglik)

    def step(self, inputs: Mapping[str, Any]) -> dict[str, np.ndarray]:
        """Consume the current sample, return :meth:`outputs`, advance."""
        loglik = self._loglik
        return self._as_dict(self._advance(self._compute(inputs)[1]), loglik)

    def get_state(self) -> dict[str, Any]:
        st = self._state
        return {"x": st.x.copy(), "P": st.P.copy(), "t": int(st.t), "log_likelihood": float(self._loglik)}

    def set_state(self, state: Mapping[str, Any]) -> None:
        n = self._km.nx
        try:
            x = as_vector(state["x"], "state x", n)
            P = as_matrix(state["P"], "state P", (n, n))
            t = int(state["t"])
            ll = float(state["log_likelihood"])
        except KeyError as exc:
            raise DimensionError(f"state is missing {exc.args[0]!r}") from None
        P = check_positive_definite(P, "state P", semidefinite=True)
        if t < 0:
            raise DimensionError(f"state t = {t} is negative")
        if not math.isfinite(ll):
            raise NonFiniteError(f"state log_likelihood is {ll}")
        x.setflags(write=False)
        P.setflags(write=False)
        self._state = KalmanState(x, P, t)
        self._loglik = ll
        self._pending = None
