"""The solve: identifiability (rank) check, the optional P-spline penalty (given or by GCV),
the estimated coefficients and outputs (:func:`fit_kernel_model`, :func:`kernel_regression`).

Notes: :mod:`lpvest.estimators.bspline`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ...core._errors import (
    DimensionError,
    IdentifiabilityError,
    NonFiniteError,
    abbreviate,
)
from ...core._validation import as_vector
from ...systems._ltv import LTVInputOutput, TimeFunction
from ._kernels import (
    check_uniform_samples as _check_samples,
    coefficient_terms,
    finish_identity,
    slot_derivative,
    slot_identity,
)
from ._model import KernelModel
from ._regression import (
    SIGNAL_OF,
    KernelParts,
    RegressionPlan,
    build_plan,
    compressed_system,
    dense_system,
    kernel_parts,
)

__all__ = [
    "KernelFit",
    "fit_window",
    "check_options",
    "fit_kernel_model",
    "observer_supports",
    "KernelRegression",
    "kernel_regression",
]


# -- the solve -----------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class KernelFit:
    """The result of :func:`fit_kernel_model` on one window ``[a, b]``.

    Parameters
    ----------
    t : ndarray, shape (m,)
        Sample times.
    window : tuple of float
        ``(a, b)``.
    y, dy : ndarray, shape (m,)
        ``y_E`` from (9) and ``y_E'`` from the derivative identity (10), with
        the estimated coefficients.
    x : ndarray, shape (m, 2)
        State of the realization :meth:`LTVInputOutput.to_state_space`
        (``x_1 = y``, ``x_2 = y' + b_1 u``), (32).
    values : dict of str to ndarray, shape (m,)
        ``a0, a1, b0, b1`` (known or estimated) at the samples.
    coefficients : dict of str to TimeFunction
        All four coefficients as functions of time (estimated splines as
        scipy ``BSpline`` objects with their exact derivative).
    constants : dict of str to float
        The estimated unknown constants.
    splines : dict of str to scipy.interpolate.BSpline
        The estimated B-spline coefficients (absolute time).
    beta : ndarray, shape (s,)
        All unknown scalar coefficients, labelled by ``labels``.
    labels : tuple of str
        ``"a0[k]"`` for spline coefficients, ``"a1"`` for a constant.
    residual_rms : float
        Root mean square of ``q - P beta`` over the regression instants.
    penalty : float
        Penalty weight ``lambda`` used (0: plain least squares).
    edf : float
        Effective degrees of freedom (trace of the hat matrix; ``s`` without penalty).
    gcv : float
        GCV score ``m * RSS / (m - edf)^2`` at ``penalty``.
    singular_values : ndarray, shape (s,)
        Singular values of the column-scaled ``P`` (identifiability margin).
    instants : ndarray of int
        Sample indices used as regression instants.
    """

    t: np.ndarray
    window: tuple[float, float]
    y: np.ndarray
    dy: np.ndarray
    x: np.ndarray
    values: dict[str, np.ndarray]
    coefficients: dict[str, TimeFunction]
    constants: dict[str, float]
    splines: dict[str, object]
    beta: np.ndarray
    labels: tuple[str, ...]
    residual_rms: float
    penalty: float
    edf: float
    gcv: float
    singular_values: np.ndarray
    instants: np.ndarray

    @property
    def condition(self) -> float:
        """Condition number of the column-scaled ``P``."""
        return float(self.singular_values[0] / self.singular_values[-1])


def _instant_indices(instants: object, m: int) -> np.ndarray:
    if instants is None:
        return np.arange(m)
    if isinstance(instants, int | np.integer) and not isinstance(instants, bool):
        if instants < 1:
            raise DimensionError(f"instants (a stride) must be >= 1; found {instants}")
        return np.arange(0, m, int(instants))
    idx = np.asarray(instants)
    if idx.ndim != 1 or idx.dtype.kind not in "iu":
        raise DimensionError(f"instants must be None, a stride or a 1-D array of sample indices; found "
                             f"{abbreviate(instants, 30)}")
    if idx.size and (idx.min() < 0 or idx.max() >= m):
        raise DimensionError(f"instants hold sample indices outside [0, {m - 1}]")
    if np.unique(idx).size != idx.size:
        raise DimensionError("instants must be distinct sample indices")
    return np.sort(idx)


def _unidentifiable_message(plan: RegressionPlan, participation: np.ndarray, reason: str) -> str:
    names = []
    for block in plan.blocks:
        part = participation[block.col : block.col + block.size]
        if np.any(part):
            if block.spline is None:
                names.append(block.name)
            else:
                idx = np.flatnonzero(part)
                which = ", ".join(str(i) for i in idx[:8]) + (", ..." if idx.size > 8 else "")
                names.append(f"{block.name} (B-spline basis functions {which})")
    return f"{reason}; the data do not determine: {'; '.join(names)} (practical identifiability, Definition 1)"


def _check_excitation(plan: RegressionPlan, u: np.ndarray, y: np.ndarray) -> None:
    """The coefficients of a signal that is zero (to round-off, relative to its
    own peak) on every sample farther than one interpolation stencil from the
    window's ends are not determined by the data.

    Every kernel vanishes at both ends (as ``s^2``, ``r^2`` for ``a_0``, ``b_0``
    and as ``s``, ``r`` for ``a_1``, ``b_1``), and within a stencil of an end
    the quadrature sees the signal only through the interpolation of those few
    samples: such a column of ``P`` is nonzero (about ``(h / L)^2`` of a
    column of a signal spread over the window, so the rank test of the scaled
    ``P`` passes it) but it is quadrature error, not information. Example: an
    input nonzero at the last sample only (an input switched on as the window
    ends) gave ``b0 = -0.006`` for a true ``-9``.
    """
    m, edge = plan.m, plan.quad.points
    eps = np.finfo(float).eps
    for letter, name, v in (("a", "output y", y), ("b", "input u", u)):
        names = [b.name for b in plan.blocks if b.name[0] == letter]
        peak = float(np.max(np.abs(v))) if v.size else 0.0
        if not names or peak == 0.0:  # a zero signal: its columns of P are zero, reported below
            continue
        interior = float(np.max(np.abs(v[edge : m - edge]))) if m > 2 * edge else 0.0
        if interior <= m * eps * peak:
            raise IdentifiabilityError(
                f"the {name} is zero except within {edge} samples of the window's ends (where the kernels "
                f"vanish; what remains there is quadrature error); the data do not determine: "
                f"{', '.join(names)} (practical identifiability, Definition 1)"
            )


def _rank_check(plan: RegressionPlan, R: np.ndarray, rtol: float) -> np.ndarray:
    """Singular values of the scaled ``P`` (from its R factor); raise when the rank is deficient."""
    s = R.shape[1]
    sv = np.linalg.svd(R, compute_uv=False)
    if sv[-1] <= rtol * sv[0]:
        _, sv, vt = np.linalg.svd(R)  # the null space names the coefficients
        null = vt[sv <= rtol * sv[0]]
        part = np.max(null**2, axis=0) > 0.05 / s
        raise IdentifiabilityError(
            _unidentifiable_message(
                plan, part, f"rank P = {int(np.sum(sv > rtol * sv[0]))} < {s} unknowns "
                f"(singular value ratio {sv[-1] / sv[0]:.3g} <= rank_rtol = {rtol:g})"
            )
        )
    return sv


def _penalized_solve(R: np.ndarray, z: np.ndarray, D: np.ndarray, lam: float) -> tuple[np.ndarray, float]:
    """Minimise ``|z - R g|^2 + lam |D g|^2``; return ``g`` and the trace of the hat matrix."""
    from scipy.linalg import solve_triangular

    s = R.shape[1]
    if lam == 0.0 or D.shape[0] == 0:
        return solve_triangular(R, z), float(s)
    M = np.vstack([R, np.sqrt(lam) * D])
    Q2, R2 = np.linalg.qr(M)
    g = solve_triangular(R2, Q2[:s].T @ z)
    return g, float(np.sum(Q2[:s] ** 2))


def _choose_penalty(R: np.ndarray, z: np.ndarray, rho2: float, D: np.ndarray, m: int) -> float:
    """The GCV choice of lambda: a log grid, then golden-section refinement.

    The score comes from one SVD (Demmler-Reinsch form): with ``h = R g`` the
    problem is ``min |z - h|^2 + lam |S h|^2``, ``S = D R^-1 = U diag(sigma) V^T``,
    so in the coordinates ``V^T`` each component of ``V^T z`` is shrunk by
    ``1 / (1 + lam sigma_i^2)``: the residual and the trace of the hat matrix
    are sums over ``i``, O(s) per lambda. (The fit at the chosen lambda is then
    solved by :func:`_penalized_solve`, a QR.)
    """
    from scipy.linalg import solve_triangular

    s = R.shape[1]
    scale = float(np.sum(R**2) / max(np.sum(D**2), 1e-300))
    sigma2 = np.zeros(s)
    zhat2 = z**2
    if D.shape[0]:
        V, sigma, _ = np.linalg.svd(solve_triangular(R, D.T, trans="T"))  # S^T = V diag(sigma) U^T
        sigma2[: sigma.size] = sigma**2
        zhat2 = (V.T @ z) ** 2

    def gcv(log_lam: float) -> float:
        keep = 1.0 / (1.0 + scale * 10.0**log_lam * sigma2)
        rss = float(np.sum((1.0 - keep) ** 2 * zhat2)) + rho2
        edf = float(np.sum(keep))
        return m * rss / max(m - edf, 1e-12) ** 2

    grid = np.linspace(-14.0, 4.0, 37)
    scores = np.array([gcv(v) for v in grid])
    k = int(np.argmin(scores))
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
    ratio = (np.sqrt(5.0) - 1.0) / 2.0
    c, d = hi - ratio * (hi - lo), lo + ratio * (hi - lo)
    fc, fd = gcv(c), gcv(d)
    for _ in range(30):
        if fc < fd:
            hi, d, fd = d, c, fc
            c = hi - ratio * (hi - lo)
            fc = gcv(c)
        else:
            lo, c, fc = c, d, fd
            d = lo + ratio * (hi - lo)
            fd = gcv(d)
    best = min([(fc, c), (fd, d), (scores[k], grid[k])])
    return scale * 10.0 ** best[1]


def _combine(values: np.ndarray, coef: np.ndarray) -> np.ndarray:
    """``sum_r values[r] * coef[r]`` over the rows of (order, N) arrays."""
    out = values[0] * coef[0]
    for r in range(1, values.shape[0]):
        out += values[r] * coef[r]
    return out


def _fitted(
    plan: RegressionPlan, terms: KernelParts, beta: np.ndarray, u: np.ndarray
) -> tuple[dict[str, np.ndarray], dict[str, TimeFunction], dict[str, float], dict[str, object], np.ndarray, np.ndarray]:
    """Every coefficient (known or estimated) at the samples and as a function,
    and ``y_E``, ``y_E'`` from (9), (10) with the estimated coefficients."""
    from scipy.interpolate import BSpline

    quad = terms.quad
    t = quad.samples
    T, R = t - quad.a, quad.b - t
    sample_values = {name: f(t) for name, f in terms.functions.items()}
    functions = dict(terms.functions)
    constants: dict[str, float] = {}
    splines: dict[str, object] = {}
    ident = terms.known_ident.copy()
    deriv = terms.known_deriv.copy()
    for block in plan.blocks:
        coef = beta[block.col : block.col + block.size]
        order = int(block.name[1])
        if block.spline is None:
            value = float(coef[0])
            constants[block.name] = value
            sample_values[block.name] = np.full(quad.m, value)
            functions[block.name] = TimeFunction.of(value)
            F, B = terms.moments[SIGNAL_OF[block.name[0]]]
            ident += value * slot_identity(order, F, B, T, R)
            deriv += value * slot_derivative(order, F, B)
            continue
        assert block.piece_first is not None and block.values is not None and block.knots is not None
        k = block.spline.order
        # the coefficients of the non-zero B-splines at each node
        q = quad.nodes_per_piece
        at_pieces = coef[block.piece_first + np.arange(k)[:, None]]  # (k, P)
        phi = _combine(block.values.reshape(k, q, -1), at_pieces[:, None]).ravel()
        dphi = None
        if block.dvalues is not None:
            dphi = _combine(block.dvalues.reshape(k, q, -1), at_pieces[:, None]).ravel()
        v_nodes = terms.y_nodes if block.name[0] == "a" else terms.u_nodes
        di, dd = coefficient_terms(quad, order, phi, dphi, v_nodes)
        ident += di
        deriv += dd
        assert block.sample_first is not None and block.sample_values is not None
        sample_values[block.name] = _combine(block.sample_values, coef[block.sample_first + np.arange(k)[:, None]])
        spline = BSpline(block.knots + quad.a, coef.copy(), k - 1, extrapolate=True)
        splines[block.name] = spline
        # (order 1: piecewise constant, derivative zero between the knots)
        derivative = spline.derivative() if k > 1 else (lambda x: np.zeros_like(np.asarray(x, dtype=float)))
        functions[block.name] = TimeFunction.from_callable(
            spline, derivative=derivative, name=f"B-spline estimate of {block.name}"
        )
    y_e, dy_e = finish_identity(quad, ident, deriv, sample_values["a1"], sample_values["b1"], u)
    return sample_values, functions, constants, splines, y_e, dy_e


def fit_window(
    plan: RegressionPlan,
    a: float,
    u: np.ndarray,
    y: np.ndarray,
    *,
    penalty: float | str | None,
    instants: np.ndarray,
    rank_rtol: float,
) -> KernelFit:
    """Fit one window with a prepared plan: (28)-(32) for validated data.

    The work of :func:`fit_kernel_model` after validation; the sliding
    observer calls it for every refit with one plan.

    Parameters
    ----------
    plan : RegressionPlan
        From :func:`~lpvest.estimators.bspline._fit.build_plan` for ``m`` samples.
    a : float
        Time of the window's first sample.
    u, y : ndarray, shape (m,)
        Input and output samples (finite).
    penalty : None, float or str
        None or 0: plain least squares; a number: ``lambda``; a string
        (``"gcv"``, checked by :func:`check_options`): ``lambda`` by GCV.
    instants : ndarray of int
        Sorted, distinct sample indices of the regression instants.
    rank_rtol : float
        Relative singular-value threshold of the rank test.

    Returns
    -------
    KernelFit
        The estimates on ``[a, a + (m - 1) h]``.

    Raises
    ------
    IdentifiabilityError
        A signal is zero away from the window's ends, fewer instants than
        unknowns, zero columns or ``rank P`` below the number of unknowns.
    NonFiniteError
        The regression holds non-finite values (a known coefficient with a
        pole in the window).
    """
    from scipy.linalg import qr

    _check_excitation(plan, u, y)
    parts = kernel_parts(plan, a, u, y)
    s = plan.n_unknowns
    mi = instants.size
    if mi < s:
        raise IdentifiabilityError(
            f"{mi} regression instants for {s} unknown coefficients: need at least {s} (Definition 1, m >= 2n)"
        )
    A = compressed_system(plan, parts, None if mi == plan.m else instants)
    scale = np.sqrt(np.einsum("ij,ij->j", A[:, :s], A[:, :s]))
    if not (np.all(np.isfinite(scale)) and np.all(np.isfinite(A[:, s]))):
        raise NonFiniteError(
            "the kernel regression holds non-finite values: check that the known coefficients are finite on "
            f"the window [{parts.quad.a:.6g}, {parts.quad.b:.6g}]"
        )
    tiny = scale <= 1e-300 + 1e-14 * float(np.max(scale))
    if np.any(tiny):
        raise IdentifiabilityError(
            _unidentifiable_message(plan, tiny, "columns of P are zero (the data do not excite these coefficients)")
        )
    A[:, :s] /= scale
    (_, _), Raug = qr(A, mode="raw", overwrite_a=True, check_finite=False)
    R = Raug[:s, :s]
    z = Raug[:s, s]
    rho2 = float(Raug[s, s] ** 2) if Raug.shape[0] > s else 0.0
    sv = _rank_check(plan, R, rank_rtol)
    D = plan.penalty_matrix / scale
    if penalty is None or penalty == 0.0:
        lam = 0.0
    elif isinstance(penalty, str):
        lam = _choose_penalty(R, z, rho2, D, mi)
    else:
        lam = float(penalty)
    g, edf = _penalized_solve(R, z, D, lam)
    rss = float(np.sum((z - R @ g) ** 2)) + rho2
    gcv = mi * rss / max(mi - edf, 1e-12) ** 2
    beta = g / scale
    values, functions, constants, splines, y_e, dy_e = _fitted(plan, parts, beta, u)
    x = np.column_stack([y_e, dy_e + values["b1"] * u])
    return KernelFit(
        t=parts.quad.samples,
        window=(parts.quad.a, parts.quad.b),
        y=y_e,
        dy=dy_e,
        x=x,
        values=values,
        coefficients=functions,
        constants=constants,
        splines=splines,
        beta=beta,
        labels=plan.labels,
        residual_rms=float(np.sqrt(rss / mi)),
        penalty=lam,
        edf=edf,
        gcv=float(gcv),
        singular_values=sv,
        instants=instants,
    )


def check_options(penalty: object, difference_order: int, rank_rtol: float) -> None:
    """Validate the solver options of :func:`fit_kernel_model` and :class:`BSplineObserver`.

    Parameters
    ----------
    penalty : object
        Must be None, ``"gcv"`` or a finite number ``>= 0``.
    difference_order : int
        Must be an integer ``>= 1``.
    rank_rtol : float
        Must lie in ``(0, 1)``.

    Raises
    ------
    DimensionError
        An option is out of range or of the wrong type.
    """
    if penalty is not None and not (isinstance(penalty, str) and penalty == "gcv"):
        if (isinstance(penalty, bool | np.bool_) or not isinstance(penalty, int | float | np.integer | np.floating)
                or not np.isfinite(penalty) or penalty < 0):
            raise DimensionError(f"penalty must be None, 'gcv' or a finite lambda >= 0; found "
                                 f"{abbreviate(penalty, 30)}")
    if isinstance(difference_order, bool) or not isinstance(difference_order, int) or difference_order < 1:
        raise DimensionError(f"difference_order must be an integer >= 1; found {abbreviate(difference_order, 30)}")
    if not 0 < rank_rtol < 1:
        raise DimensionError(f"rank_rtol must lie in (0, 1); found {abbreviate(rank_rtol, 30)}")


def fit_kernel_model(
    model: KernelModel,
    t: object,
    u: object,
    y: object,
    *,
    penalty: float | str | None = None,
    difference_order: int = 2,
    instants: int | Sequence[int] | np.ndarray | None = None,
    points: int = 6,
    rank_rtol: float = 1e-9,
) -> KernelFit:
    """Estimate the unknown coefficients and the state on one window, (28)-(32).

    Parameters
    ----------
    model : KernelModel
        Which coefficients are known, constant or B-splines.
    t : array_like, shape (m,)
        Uniformly spaced sample times; the estimation window is ``[t[0], t[-1]]``.
    u, y : array_like, shape (m,)
        Known input and measured output at ``t``.
    penalty : None, float or "gcv", optional
        P-spline penalty: the objective is
        ``sum_j (q_j - P_j beta)^2 + lambda * sum |Delta^d beta_spline|^2`` over
        the regression instants and the B-spline blocks (constants are not
        penalised). ``None`` (default): plain least squares; a number: that
        ``lambda``; ``"gcv"``: ``lambda`` minimising the GCV score.
    difference_order : int, optional
        ``d`` of the difference penalty (default 2).
    instants : None, int or array of int, optional
        Regression instants: every sample (default), every k-th sample, or
        these sample indices.
    points : int, optional
        Order of the cumulative product quadrature (even, default 6; see
        :mod:`lpvest.estimators.bspline`).
    rank_rtol : float, optional
        ``P`` (column-scaled) is rank deficient when its smallest singular
        value is at most ``rank_rtol`` times the largest.

    Returns
    -------
    KernelFit
        The estimates, the fitted output and state, and the fit diagnostics.

    Raises
    ------
    NonFiniteError
        NaN or inf in ``t``, ``u`` or ``y``.
    SamplingError
        ``t`` not strictly increasing or not uniformly spaced.
    DimensionError
        Wrong lengths, or fewer samples than the quadrature stencil.
    IdentifiabilityError
        Fewer regression instants than unknowns, or ``rank P`` below the
        number of unknowns (Definition 1); the message names the coefficients.

    Examples
    --------
    >>> import numpy as np
    >>> from lpvest.estimators.bspline import KernelModel, UnknownConstant
    >>> t = np.linspace(0.0, 6.0, 3001)
    >>> y = np.exp(-0.5 * t) * np.sin(2 * t)     # y'' + y' + 4.25 y = 0
    >>> fit = fit_kernel_model(KernelModel(a0=UnknownConstant(), a1=UnknownConstant()), t, 0 * t, y)
    >>> round(fit.constants["a0"], 8), round(fit.constants["a1"], 8)
    (4.25, 1.0)
    """
    if not isinstance(model, KernelModel):
        raise DimensionError(f"model must be a KernelModel; found {type(model).__name__}")
    check_options(penalty, difference_order, rank_rtol)
    times, h = _check_samples(t, "t")
    uu = as_vector(u, "u", times.size)
    yy = as_vector(y, "y", times.size)
    if not model.unknowns:
        raise IdentifiabilityError("the model has no unknown coefficient: nothing to estimate")
    plan = build_plan(model, times.size, h, points=points, difference_order=difference_order)
    idx = _instant_indices(instants, times.size)
    return fit_window(plan, float(times[0]), uu, yy, penalty=penalty, instants=idx, rank_rtol=rank_rtol)


def observer_supports(model: object) -> str | None:
    """Why :class:`BSplineObserver` cannot estimate ``model`` (``None`` when
    it can): the kernel identity (9) is for second-order input-output models.

    Parameters
    ----------
    model : object
        A system model (e.g. from :func:`lpvest.load_system`).

    Returns
    -------
    str or None
        The reason, or None when ``model`` is a second-order
        :class:`~lpvest.systems.LTVInputOutput`.
    """
    if not isinstance(model, LTVInputOutput):
        return f"the B-spline observer needs an ltv-io model, not a {type(model).__name__}"
    if model.order != 2:
        return f"the B-spline observer is for second-order models (11); this one has order {model.order}"
    return None


class KernelRegression(NamedTuple):
    """The linear system (29)-(30) ``q = P beta`` at every sample.

    Parameters
    ----------
    t : ndarray, shape (m,)
        Sample times.
    P : ndarray, shape (m, s)
        Kernel integrals of the basis functions, divided by C.
    q : ndarray, shape (m,)
        ``y - r_0 / C`` (known part on the left-hand side).
    labels : tuple of str, length s
        The unknown each column multiplies (``"a0[k]"``, ``"a1"``, ...).
    """

    t: np.ndarray
    P: np.ndarray
    q: np.ndarray
    labels: tuple[str, ...]


def kernel_regression(
    model: KernelModel, t: object, u: object, y: object, *, points: int = 6
) -> KernelRegression:
    """The regression matrix ``P`` and target ``q`` of (29)-(30), dense.

    :func:`fit_kernel_model` never forms ``P`` (it reduces it segment by
    segment); this is for inspection and for checking the solve.

    Parameters
    ----------
    model : KernelModel
        Which coefficients are known, constant or B-splines (at least one unknown).
    t : array_like, shape (m,)
        Uniformly spaced sample times; the window is ``[t[0], t[-1]]``.
    u, y : array_like, shape (m,)
        Known input and measured output at ``t``.
    points : int, default 6
        Order of the cumulative product quadrature (even; see
        :mod:`lpvest.estimators.bspline`).

    Returns
    -------
    KernelRegression
        ``t``, the dense ``P``, ``q`` and the column labels.

    Raises
    ------
    IdentifiabilityError
        The model has no unknown coefficient.

    Examples
    --------
    >>> import numpy as np
    >>> from lpvest.estimators.bspline import KernelModel, UnknownConstant
    >>> t = np.linspace(0.0, 6.0, 601)
    >>> y = np.exp(-0.5 * t) * np.sin(2 * t)     # y'' + y' + 4.25 y = 0
    >>> reg = kernel_regression(KernelModel(a0=UnknownConstant(), a1=1.0), t, 0 * t, y)
    >>> reg.P.shape, reg.labels
    ((601, 1), ('a0',))
    >>> beta = np.linalg.lstsq(reg.P, reg.q, rcond=None)[0]
    >>> round(float(beta[0]), 8)
    4.25
    """
    if not isinstance(model, KernelModel):
        raise DimensionError(f"model must be a KernelModel; found {type(model).__name__}")
    times, h = _check_samples(t, "t")
    uu = as_vector(u, "u", times.size)
    yy = as_vector(y, "y", times.size)
    if not model.unknowns:
        raise IdentifiabilityError("the model has no unknown coefficient: nothing to estimate")
    plan = build_plan(model, times.size, h, points=points, difference_order=2)
    A = dense_system(plan, kernel_parts(plan, float(times[0]), uu, yy))
    s = plan.n_unknowns
    return KernelRegression(plan.quad.shifted(float(times[0])).samples, np.ascontiguousarray(A[:, :s]),
                            A[:, s].copy(), plan.labels)


