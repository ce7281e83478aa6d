"""The p-dependent matrices of the Kalman recursion: :class:`KalmanModel` compiles an
:class:`~lpvest.systems.AffineLPV` into the coefficients of one product ``z(p) @ coefficients``
per sample (notes: :mod:`lpvest.estimators.kalman`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, NamedTuple, TypedDict

import numpy as np

from ...core._errors import ArgumentTypeError, DimensionError
from ...core._validation import as_matrix, as_signal, as_vector, check_positive_definite
from ...systems._affine import AffineLPV, NoiseCovariance

if TYPE_CHECKING:
    from ...core._scheduling import BasisFunction

__all__ = ["KalmanMatrices", "StepMatrices", "KalmanModel"]

# ---------------------------------------------------------------------------
# p-dependent matrices
# ---------------------------------------------------------------------------
class KalmanMatrices(NamedTuple):
    """The p-dependent matrices of (4c)-(4e) at one sample, or stacked along
    time (leading axis ``T``).

    ``GQG = G Q G^T`` (n_x, n_x), ``GSH = G S H^T`` (n_x, n_y),
    ``HRH = H R H^T`` (n_y, n_y); ``A, B, C, D`` as in (1).

    Parameters
    ----------
    A : ndarray, shape (n_x, n_x) or (T, n_x, n_x)
        ``A(p)`` of (1).
    B : ndarray, shape (n_x, n_u) or (T, n_x, n_u)
        ``B(p)`` of (1).
    C : ndarray, shape (n_y, n_x) or (T, n_y, n_x)
        ``C(p)`` of (1).
    D : ndarray, shape (n_y, n_u) or (T, n_y, n_u)
        ``D(p)`` of (1).
    GQG : ndarray, shape (n_x, n_x) or (T, n_x, n_x)
        ``G Q G^T``, the state noise covariance of (4d).
    GSH : ndarray, shape (n_x, n_y) or (T, n_x, n_y)
        ``G S H^T``, the cross-covariance of (4c).
    HRH : ndarray, shape (n_y, n_y) or (T, n_y, n_y)
        ``H R H^T``, the measurement noise covariance of (4e).
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

    Parameters
    ----------
    F : ndarray, shape (2 n_x + n_y, 3 n_x + n_u + n_y) or (T, 2 n_x + n_y, 3 n_x + n_u + n_y)
        The packed matrix above (one sample, or a stack along time).
    nx : int
        ``n_x``, the state dimension.
    nu : int
        ``n_u``, the input dimension (0: no input; ``B``, ``D`` have no columns).
    ny : int
        ``n_y``, the output dimension.
    """

    F: np.ndarray
    nx: int
    nu: int
    ny: int

    def readable(self) -> KalmanMatrices:
        """The same matrices as :class:`KalmanMatrices` (views).

        Returns
        -------
        KalmanMatrices
            Views into :attr:`F`, stacked like it (no copy).
        """
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
        """Sample ``t`` of a stack.

        Parameters
        ----------
        t : int
            Index along the leading (time) axis of the stack.

        Returns
        -------
        StepMatrices
            The matrices of that sample (``F`` a view, unstacked).
        """
        return StepMatrices(self.F[t], self.nx, self.nu, self.ny)

    def window(self, start: int, stop: int) -> StepMatrices:
        """Samples ``start..stop-1`` of a stack.

        Parameters
        ----------
        start : int
            First sample (index along the leading axis).
        stop : int
            One past the last sample.

        Returns
        -------
        StepMatrices
            A stack of ``stop - start`` samples (``F`` a view).
        """
        return StepMatrices(self.F[start:stop], self.nx, self.nu, self.ny)


def _monomial_pairs(k: int) -> list[tuple[int, int]]:
    """Products ``psi_i psi_j`` (1 <= i <= j <= k) in the order of ``z``."""
    return [(i, j) for i in range(1, k + 1) for j in range(i, k + 1)]


class _Compiled(TypedDict):
    """What :meth:`KalmanModel._compile` computes once (``KalmanModel._c``)."""

    packed: np.ndarray  #: (n_z, rows * cols): the coefficients of the packed matrix F
    plain: np.ndarray  #: (n_z, ...): A, B, C, D, G Q G^T, G S H^T, H R H^T side by side
    plain_shapes: list[tuple[int, ...]]  #: their shapes
    scan: np.ndarray  #: plain followed by A^T
    shape: tuple[int, int]  #: the shape of F
    pairs: list[tuple[int, int]]  #: the products psi_i psi_j in z (1-based)
    k: int  #: number of basis functions
    basis: tuple[BasisFunction, ...]
    exponents: list[tuple[int, ...]] | None  #: every psi_i a monomial: its exponents
    components: list[int] | None  #: every psi_i = p_j: the j
    lo: list[float]  #: the scheduling box, widened by the tolerance
    hi: list[float]


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
        The affine LPV model (1)-(3) to compile.
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
    if TYPE_CHECKING:  # not a field: set by _compile (a frozen class); declared for the type checker only
        _c: _Compiled = field(init=False, repr=False)

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
        from ...core._scheduling import Monomial

        monomials = [b for b in basis if isinstance(b, Monomial)]
        monomial = len(monomials) == len(basis)
        # the common case psi_i(p) = p_j: read the components directly
        components = None
        if monomial and all(sorted(b.exponents) == [0] * (len(b.exponents) - 1) + [1] for b in monomials):
            components = [b.exponents.index(1) for b in monomials]
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
                "exponents": [b.exponents for b in monomials] if monomial else None,
                "components": components,
                "lo": (space.lower - tol).tolist(),
                "hi": (space.upper + tol).tolist(),
            },
        )

    @property
    def packing(self) -> tuple[np.ndarray, tuple[tuple[int, int], ...], tuple[int, int]]:
        """How one sample's packed matrix is computed: ``F(p) = (z(p) @ packed).reshape(shape)``
        with ``z = [1, psi_1, ..., psi_k, psi_i psi_j for (i, j) in pairs]``
        (1-based ``i <= j``); the native backend carries these numbers.

        Returns
        -------
        packed : ndarray, shape (n_z, rows * cols)
            The coefficients (read-only).
        pairs : tuple of (int, int)
            The products of basis functions in ``z``, in order.
        shape : (int, int)
            ``(2 n_x + n_y, 3 n_x + n_u + n_y)``.
        """
        c = self._c
        return c["packed"], tuple(c["pairs"]), c["shape"]

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
        """Raise :class:`~lpvest.core.SchedulingRangeError` if ``p`` (a finite
        float vector of the right length) lies outside the box.

        Each bound is widened by ``1e-12 max(1, |lower|, |upper|)`` (rounding),
        as in the scheduling space's own check, which raises the error.

        Parameters
        ----------
        p : ndarray, shape (n_p,)
            Scheduling vector ``p_t``, already validated (finite floats).
        t : int, optional
            Time index, named in the error message (default: none named).

        Raises
        ------
        SchedulingRangeError
            ``p`` lies outside the scheduling box.
        """
        c = self._c
        for v, lo, hi in zip(p.tolist(), c["lo"], c["hi"], strict=True):
            if v < lo or v > hi:
                what = "scheduling value" if t is None else f"scheduling value at t={t}:"
                self.model.space.check(p, what=what)  # raises with the standard message

    def z(self, p: np.ndarray) -> list[float]:
        """``z(p) = [1, psi_1, ..., psi_k, psi_i psi_j (i <= j)]``.

        Parameters
        ----------
        p : ndarray, shape (n_p,)
            Scheduling vector (floats; not checked).

        Returns
        -------
        z : list of float, length n_z
            ``n_z = 1 + k + k (k + 1) / 2`` for ``k`` basis functions ``psi_i``.
        """
        c = self._c
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
        """``z`` along a trajectory ``p`` (T, n_p): shape (T, n_z).

        Parameters
        ----------
        p : ndarray, shape (T, n_p)
            Scheduling trajectory (floats; not checked).

        Returns
        -------
        z : ndarray, shape (T, n_z)
            Row ``t`` is :meth:`z` at ``p[t]``.
        """
        c = self._c
        T = p.shape[0]
        psi = np.empty((T, c["k"]))
        for i, b in enumerate(c["basis"]):
            psi[:, i] = b.evaluate(p)
        cols = [np.ones((T, 1)), psi] + [psi[:, i - 1 : i] * psi[:, j - 1 : j] for i, j in c["pairs"]]
        return np.concatenate(cols, axis=1)

    def step_matrices(self, p: object, *, check: bool = True) -> StepMatrices:
        """:class:`StepMatrices` at one scheduling vector ``p`` (n_p,).

        Parameters
        ----------
        p : array_like, shape (n_p,)
            Scheduling vector ``p_t`` (validated: finite, right length).
        check : bool, default True
            Range-check ``p`` against the scheduling box (:meth:`check_p`).

        Returns
        -------
        StepMatrices
            The packed matrices of the recursion at ``p``.
        """
        pv = as_vector(p, "p", self.n_p)
        if check:
            self.check_p(pv)
        return self.step_matrices_unchecked(pv)

    def step_matrices_unchecked(self, p: np.ndarray) -> StepMatrices:
        """:class:`StepMatrices` at a ``p`` (n_p,) float array already checked (the streaming filters).

        Parameters
        ----------
        p : ndarray, shape (n_p,)
            Scheduling vector, already validated and range-checked.

        Returns
        -------
        StepMatrices
            The packed matrices of the recursion at ``p``.
        """
        c = self._c
        return StepMatrices(np.dot(self.z(p), c["packed"]).reshape(c["shape"]), self.nx, self.nu, self.ny)

    def step_matrices_batch(self, p: np.ndarray, *, check: bool = True) -> StepMatrices:
        """:class:`StepMatrices` stacked along a trajectory ``p`` (T, n_p).

        Parameters
        ----------
        p : array_like, shape (T, n_p)
            Scheduling trajectory (validated: finite, ``n_p`` columns).
        check : bool, default True
            Range-check every sample (:meth:`check_box_batch`).

        Returns
        -------
        StepMatrices
            ``F`` of shape (T, 2 n_x + n_y, 3 n_x + n_u + n_y).
        """
        p = as_signal(p, "p", self.n_p)
        if check:
            self.check_box_batch(p)
        c = self._c
        F = (self.z_batch(p) @ c["packed"]).reshape(p.shape[0], *c["shape"])
        return StepMatrices(F, self.nx, self.nu, self.ny)

    def check_box_batch(self, p: np.ndarray) -> None:
        """Range-check a trajectory (T, n_p); the error names the first bad ``t``.

        Parameters
        ----------
        p : ndarray, shape (T, n_p)
            Scheduling trajectory, already validated (finite floats).

        Raises
        ------
        SchedulingRangeError
            Some ``p[t]`` lies outside the scheduling box (widened as in
            :meth:`check_p`).
        """
        c = self._c
        bad = np.any((p < np.asarray(c["lo"])) | (p > np.asarray(c["hi"])), axis=1)
        if np.any(bad):
            t = int(np.argmax(bad))
            self.model.space.check(p[t], what=f"scheduling value at t={t}:")

    def matrices(self, p: object, *, check: bool = True) -> KalmanMatrices:
        """:class:`KalmanMatrices` at one scheduling vector ``p``.

        Parameters
        ----------
        p : array_like, shape (n_p,)
            Scheduling vector ``p_t`` (validated: finite, right length).
        check : bool, default True
            Range-check ``p`` against the scheduling box (:meth:`check_p`).

        Returns
        -------
        KalmanMatrices
            ``A, B, C, D, G Q G^T, G S H^T, H R H^T`` at ``p``.
        """
        pv = as_vector(p, "p", self.n_p)
        if check:
            self.check_p(pv)
        c = self._c
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
        c = self._c
        flat = self.z_batch(p) @ c["scan"]
        T = p.shape[0]
        out, pos = [], 0
        for shp in [*c["plain_shapes"], c["plain_shapes"][0]]:
            size = int(np.prod(shp))
            out.append(flat[:, pos : pos + size].reshape(T, *shp))
            pos += size
        return KalmanMatrices(*out[:-1]), out[-1]

    def matrices_batch(self, p: object, *, check: bool = True) -> KalmanMatrices:
        """:class:`KalmanMatrices` stacked along a trajectory ``p`` (T, n_p).

        Parameters
        ----------
        p : array_like, shape (T, n_p)
            Scheduling trajectory (validated: finite, ``n_p`` columns).
        check : bool, default True
            Range-check every sample (:meth:`check_box_batch`).

        Returns
        -------
        KalmanMatrices
            Every matrix stacked along time (leading axis ``T``).
        """
        p = as_signal(p, "p", self.n_p)
        if check:
            self.check_box_batch(p)
        c = self._c
        flat = self.z_batch(p) @ c["plain"]
        T = p.shape[0]
        out, pos = [], 0
        for shp in c["plain_shapes"]:
            size = int(np.prod(shp))
            out.append(flat[:, pos : pos + size].reshape(T, *shp))
            pos += size
        return KalmanMatrices(*out)


